"""Reporting, apart from the algorithm: the live progress line, the generation log and learning
curves, the adaptation figure and videos of evaluation episodes, and the experiment trackers (``loggers``:
TensorBoard, W&B, MLflow)."""
