"""The package version (its own module: modules that record it import this, not the package)."""
__version__ = '0.1.0'
