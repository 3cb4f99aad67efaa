"""The simplified model: the wheeled inverted pendulum model (WIPM) of the paper, its
parameters lambda(q) and its optimal-control problem."""
