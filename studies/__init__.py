"""The validation studies; run each as ``python -m studies.<name>``."""
