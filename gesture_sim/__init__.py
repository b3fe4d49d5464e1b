"""gesture_sim: body language from speech on a physics-simulated MuJoCo humanoid.

Pipeline (see docs/DESIGN.md): audio -> prosody -> inference (CRF belief) -> control (MDP policy)
-> joint targets -> MuJoCo physics -> viewer / video / metrics.

Where the data are found (:data:`DATA_DIR`): the humanoid (``assets/mjcf``), the example speech
(``assets/audio``) and the default motion library with its model (``motion_library/default``)
are looked up under one root, chosen once at import by this rule:

1. an installed wheel carries them inside the package, in ``gesture_sim/_data/`` (``setup.py``
   copies them there at build time): that copy is used whenever it exists;
2. otherwise (a checkout, or an editable install of one) the source tree that holds the
   package, i.e. the folder above ``gesture_sim/``.

Import side effect: without a display (no ``DISPLAY``) and without an explicit ``MUJOCO_GL``,
importing the package sets ``MUJOCO_GL=egl`` so that MuJoCo renders headless. It must happen
before :mod:`mujoco` is imported, which is why it lives here and not in the command line; a
``MUJOCO_GL`` set by the user always wins.
"""

import os
from pathlib import Path

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

__version__ = "0.1.0"

#: This package's folder.
PACKAGE_DIR = Path(__file__).resolve().parent
#: The folder above the package: the repository root in a checkout.
REPO_DIR = PACKAGE_DIR.parent
#: Package data of an installed wheel (absent in a checkout).
BUNDLED_DATA_DIR = PACKAGE_DIR / "_data"


def find_data_dir(package_dir: Path = PACKAGE_DIR) -> Path:
    """The root holding ``assets/`` and ``motion_library/`` for a package at ``package_dir``.

    The wheel's bundled copy (``package_dir/_data``) when it exists, else the folder above the
    package (a source checkout). See the module docstring.
    """
    bundled = package_dir / "_data"
    if (bundled / "assets" / "mjcf").is_dir():
        return bundled
    return package_dir.parent


#: Root of the data: ``BUNDLED_DATA_DIR`` when installed from a wheel, ``REPO_DIR`` in a checkout.
DATA_DIR = find_data_dir()
ASSETS_DIR = DATA_DIR / "assets"
MJCF_DIR = ASSETS_DIR / "mjcf"
LIBRARY_DIR = DATA_DIR / "motion_library"
DEFAULT_LIBRARY_DIR = LIBRARY_DIR / "default"
#: The shipped example speech (public domain; ``assets/audio/SOURCE.md``).
EXAMPLE_SPEECH = ASSETS_DIR / "audio" / "jfk.wav"
