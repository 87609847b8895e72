"""The spec: pydantic models of the TOML file, its loader, and the search space it defines.

This layer imports no stage: the plug-ins a spec names come in through a :class:`Catalogue`.
"""

from sweep3d.spec.catalogue import Catalogue
from sweep3d.spec.framing import Framing
from sweep3d.spec.loader import ControlInstance, LoadedSpec, load_spec
from sweep3d.spec.models import Spec
from sweep3d.spec.params import Choice, Fixed, Range, Space

__all__ = ["Catalogue", "Choice", "ControlInstance", "Fixed", "Framing", "LoadedSpec", "Range", "Space", "Spec",
           "load_spec"]
