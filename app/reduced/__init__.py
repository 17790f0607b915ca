"""The modal-reduced tier: Craig-Bampton bases of piezoelectric FE models (see docs/reduced.md)."""
