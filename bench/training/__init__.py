"""Training the learning methods, and the Q-calibration check of a trained critic."""
