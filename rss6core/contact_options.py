"""The contact level's scene options, kept apart from its solver so that reading a scene and
running the other levels never load the compiled contact kernel (and numba with it, 0.3 s of
import in every process)."""
from __future__ import annotations

__all__ = ["MAX_CONTACT_REFINEMENTS", "CONTACT_STARTS", "TOL_DISPLACEMENT", "TOL_VELOCITY"]

MAX_CONTACT_REFINEMENTS = 10   # halvings of the contact step the adaptive step may take (1/1024)
CONTACT_STARTS = ("drawn", "equilibrium")   # the contact level's initial states (contact_start.py)
TOL_DISPLACEMENT = 1e-12   # m: Newton stops when the update moves no joint by more
TOL_VELOCITY = 1e-9        # m/s: ... and changes no joint velocity by more (explicit steps)
