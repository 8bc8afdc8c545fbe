"""The ``fdbench`` command line, one module per job: ``app`` (the typer app and the contract's
error handling), ``options`` (options declared once: single ones, groups handed to a command as
one value, and the methods' options made from the registries), ``conditions`` (the motion's and
the model's options, as RunSpec fields), ``common`` (checks, rendering, writing, the store), ``runs`` (the commands of one run), ``sweeps`` (report and study) and ``store_commands`` (``fdbench
runs``: looking at stored runs), ``models_command`` (``fdbench models``: the model library) and
``osim_command`` (``fdbench import-osim``: an OpenSim model as a model file), ``peers_command``
(``fdbench peer``: OpenSim's and Moco's runs) and ``muscles_command`` (``fdbench muscles``: a model's
muscles along a motion).

Rendering with rich happens here only; heavy imports are made inside the commands so that
``fdbench --help`` is instant.
"""

from . import models_command, runs, store_commands, sweeps  # noqa: F401  (registration of the commands)
from . import osim_command  # noqa: F401,I001  (registered after the run commands: listed after them in --help)
from . import peers_command  # noqa: F401,I001
from . import muscles_command  # noqa: F401,I001
from .app import BadInput, app, main

__all__ = ["BadInput", "app", "main"]
