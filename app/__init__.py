"""piezodyn: piezoelectric actuators with contact and impact on FEniCSx."""

__version__ = "0.1.0"
