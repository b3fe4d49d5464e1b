"""The simulated humanoid: model access, PD + balance tracking, the simulation loop."""
