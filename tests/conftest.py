import os

from hypothesis import HealthCheck, settings

# Numba compiles on first use (cached afterwards): no per-example deadline. CI runs a fixed
# sequence of examples so a red run can be reproduced.
settings.register_profile("fdbench", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("ci", parent=settings.get_profile("fdbench"), derandomize=True)
settings.load_profile("ci" if os.environ.get("CI") else "fdbench")
