"""The paper's further experiments and the calibration: lateral, mixed traffic, sweeps, stalls."""
