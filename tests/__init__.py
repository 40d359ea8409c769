"""The test suite is a package so that its helpers import as `tests.<module>` (no sys.path edits)."""
