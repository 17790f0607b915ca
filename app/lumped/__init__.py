"""Lumped percussion-drill model (drill paper Section 3.2, eqs. 5-16, Fig. 11).

A 1-DOF equivalent transducer (modal mass, stiffness, damping, force factor) riding on a rigid
transducer mass, a free mass (steel ball), a drill stem and a rock surface, joined by Kelvin-Voigt
contact layers that close by coordinates and open when their force reaches zero.

Between contact events the equations are linear with sinusoidal forcing, so the integrator
propagates them exactly with cached matrix exponentials and locates events on a dyadic time
lattice (see ``docs/lumped.md``).
"""
