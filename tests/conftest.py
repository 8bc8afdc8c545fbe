import os
import signal

from hypothesis import HealthCheck, settings

# Numba compiles on first use (cached afterwards): no per-example deadline. CI runs a fixed
# sequence of examples so a red run can be reproduced.
settings.register_profile("fdbench", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("ci", parent=settings.get_profile("fdbench"), derandomize=True)
settings.load_profile("ci" if os.environ.get("CI") else "fdbench")

# A shell starts a background job (`pytest -q &`, a CI script's `&`) with Ctrl-C ignored, and an
# ignored signal stays ignored in every program it starts: the commands the tests interrupt
# would never see their SIGINT. The tests interrupt commands as a terminal's Ctrl-C does, so
# their children start with the default disposition, whatever this process inherited.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
