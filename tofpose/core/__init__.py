"""Camera, catalog, geometry and ToF physics: what every stage stands on."""
