"""Pure-JAX DDPG: networks, replay, noise, losses and the jitted train loop."""
