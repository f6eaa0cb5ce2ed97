"""The regression check: the paper's claims and the own reference on the CI cases."""
