"""The ``flexvib`` command (``studies.cli:main``) and its machinery, apart from the library: the
command line (``_main``), the plan a scene and ``--set``/``--only`` declare (``_scene.ScenePlan``),
running it into a result file (``_run``), the resource guard (``_guard``), the JIT warm-up (``_jit``),
what the terminal shows (``_console``), figures and the report (``_report``), ``flexvib animate``
(``_animate``), ``flexvib check`` (``_check``) and ``flexvib demo`` (``_demo``). The modules here
import the library (``studies._*``); no library module imports from here (the package's face,
``studies/__init__.py``, re-exports ``guard`` and ``ResourceError``)."""

from .. import _face  # noqa: F401  (the study kinds registered, as importing studies did before it was lazy)
from .._errors import UsageError as UsageError
from ._main import DEFAULT_SCENE as DEFAULT_SCENE
from ._main import load_scene as load_scene
from ._main import main as main
from ._scene import MATHIEU as MATHIEU
from ._scene import ScenePlan as ScenePlan

__all__ = ["DEFAULT_SCENE", "MATHIEU", "ScenePlan", "UsageError", "load_scene", "main"]
