"""Batch jobs on Dask, one at a time on one queue (``batch_queue``): accuracy studies
(``studies``) and re-processing of campaign recordings (``reprocessing``). Imports
nothing."""
