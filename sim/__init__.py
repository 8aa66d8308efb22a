"""The simulator: world, sensors, mapping, metrics, the episode runner and recordings."""
