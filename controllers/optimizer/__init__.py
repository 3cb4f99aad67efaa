"""The optimiser: a JAX-autodiff DDP over the WIPM (one jitted solver) and its JAX settings."""
