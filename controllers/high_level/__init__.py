"""The high level: the offline DDP plan over the whole horizon and the MPC that tracks it."""
