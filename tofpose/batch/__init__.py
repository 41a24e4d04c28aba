"""Batch work on Dask distributed: the connection to a cluster (``cluster``) and the
re-processing of recordings in chunks (``reprocess``, ``compare``)."""
