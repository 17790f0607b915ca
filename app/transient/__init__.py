"""Transient analysis: generalized-alpha time stepping of FE + rigid bodies with penalty contact.

Layers (each small, each testable alone):

- ``rigid``     rigid bodies (own DOFs, mass, gravity, applied force, prescribed motion)
- ``fe``        the linear FE part: M, C, K, loads, Dirichlet drives, factorised K_eff per dt
- ``contact``   penalty contacts: FE surface vs rigid body (UFL), rigid vs rigid (Kelvin-Voigt)
- ``coupled``   one step: FE condensed onto the contact DOFs, Newton (PETSc SNES) on contact forces + rigid DOFs
- ``impacts``   generic statistics of a run from its time series (the keys of every tier;
                scene-specific ones: app/scenes/)
- ``control``   dt by contact state (open / closed / changing), growth and cut-back
- ``stepper``   the time loop (update loads, solve, check reason, export, shift, adapt dt)
- ``checkpoint`` checkpoints for ``--resume``; ``fields`` XDMF fields (time series: app/series.py)
- ``schema``/``driver``  the ``[transient]`` case section and the runner entry point
"""
