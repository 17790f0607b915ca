"""The one outer run loop of every transient engine (FE, modal, lumped): resume-or-start, checkpoints, the
time-series writer, the steady-state stop, progress and the summary's common keys (app/loop/loop.py).
"""
