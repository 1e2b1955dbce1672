"""The ``sctd`` command line."""
