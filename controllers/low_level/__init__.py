"""The low level: the task-priority QP on the isolated manipulator dynamics (eq. iso3), its
tasks and their kernel."""
