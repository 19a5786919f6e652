"""The package version (also in pyproject.toml), on floor 0 so that `io.run_metadata` can
record it without importing the package's public face."""

__version__ = "0.1.0"
