"""Ultrasonic motor scene: stator-rotor friction drive (see docs/motor-stator.md)."""
