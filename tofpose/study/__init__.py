"""Monte-Carlo accuracy studies over the operating envelope, on Dask distributed.

``spec`` (the study's JSON: grid of cells, frames per cell, seed), ``frames`` (one
chunk of simulated frames measured and judged: the task a worker runs), ``store`` (the
per-frame Parquet store and the study's manifest), ``summary`` (per-cell statistics),
``report`` (HTML and PDF with plots), ``run`` (submit, progress, cancel).
"""
