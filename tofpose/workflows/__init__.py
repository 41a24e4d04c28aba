"""What the ``tofpose`` commands do, as library functions: ``tofpose.cli`` parses the
command line and calls these; bench scripts and tests call them directly.

- ``measurement``: estimate a recording's poses, calibrate the range and the covariance.
- ``simulation``: simulated recordings, scenario PNGs, the demo.
- ``interop``: MCAP export and import.
- ``batch``: Dask studies, re-processing and run comparison, with their console summary.
"""
