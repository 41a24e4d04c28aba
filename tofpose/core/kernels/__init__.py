"""Compiled arithmetic shared by the stages (camera model, small matrices,
statistics, pixel indexing)."""
