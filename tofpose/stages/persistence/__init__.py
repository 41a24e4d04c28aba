"""§3.2's persistence over frames and §3.4's measurement of each blob (centroid, range,
back-projection, Eqs. 7-9)."""
