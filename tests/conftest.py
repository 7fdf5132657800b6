"""Shared test set-up: a per-session DHR cache folder, so tests never touch ~/.cache."""
import os
import tempfile

# Set before any hyde_bsdf import builds or reads a DHR table.
os.environ.setdefault("HYDE_BSDF_CACHE", os.path.join(tempfile.gettempdir(), "hyde-bsdf-test-cache"))
os.environ.setdefault("MPLBACKEND", "Agg")
