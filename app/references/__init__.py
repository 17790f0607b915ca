"""Closed-form and semi-analytic references the validation cases and tests compare the tiers against (the
travelling-wave friction drive of the strip case and the motor)."""
