"""HTTP and WebSocket API: schemas, dependencies, one router per resource."""
