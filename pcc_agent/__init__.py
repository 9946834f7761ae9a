"""Controllable embeddings (PCC, E2C, RCE) and latent iLQR-MPC control."""

__version__ = "0.1.0"
