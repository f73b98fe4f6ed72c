"""Which physics engines can run on this machine, for tests that need one."""

from __future__ import annotations

import pytest

from metaopt.plugins import registry

#: Why ODE cannot run here ('' where it can): its library, libode8, comes from apt.
ODE_MISSING = registry().physics_backends["ode"].unavailable
needs_ode = pytest.mark.skipif(bool(ODE_MISSING), reason=ODE_MISSING or "ODE is installed")
