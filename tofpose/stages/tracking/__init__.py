"""Tracking mode: search windows around the predicted reflectors and the one-call
tracked frame."""
