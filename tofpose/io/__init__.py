"""Files in and out: recordings, pose CSV, camera files, MCAP and Foxglove."""
