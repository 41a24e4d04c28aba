"""tofpose backend: the FastAPI service that owns the devices and runs the pipeline live.

Nothing is created at import time; ``backend.app.create_app(settings)`` builds everything.
"""

__version__ = "0.1.0"
