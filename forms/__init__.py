"""Pure UFL physics: kinematics, constitutive laws, mass and damping, from fields and materials.

No meshes, solvers or files live here; every function maps UFL fields (and numpy/UFL material
tensors) to UFL expressions or forms.
"""
