"""Scenes shipped with skdgmpm (TOML files and their mesh files)."""
