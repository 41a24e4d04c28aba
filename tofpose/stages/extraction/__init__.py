"""§3.1-§3.2 and §3.4's measurement model: active pixels, nLoG, blob criteria, centroids
and their sigmas."""
