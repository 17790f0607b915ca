"""Finite-element model assembly shared by the modal, harmonic and transient drivers."""
