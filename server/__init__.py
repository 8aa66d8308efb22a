"""The benchmark service: FastAPI app, database models, settings, auth, artifact storage.

It never imports pybullet or Open3D at import time.
"""
