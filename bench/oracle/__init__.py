"""Energy-optimal bound: SUMO's EV energy model in numpy and a dynamic-programming oracle."""
