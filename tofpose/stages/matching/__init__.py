"""§4: deterministic-annealing matching of blobs to the catalog, the triplet search and
the rigid residual check."""
