"""Case files: TOML scenes validated into typed dataclasses before any dolfinx object exists."""
