"""The benchmark harness: fixed cases, one episode, executors, the run, shipped policies, provenance."""
