"""The baselines: the decoupled controllers of the Krang papers (Krang 2014's BAL_LO
balancing, our LQR on the plan's lean, the decoupled MPC) and their references."""
