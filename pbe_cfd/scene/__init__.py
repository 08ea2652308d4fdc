"""TOML scene files -> validated, frozen dataclasses."""
