"""The spec: pydantic models of the TOML file, its loader, and the search space it defines."""

from sweep3d.spec.loader import ControlInstance, LoadedSpec, load_spec
from sweep3d.spec.models import Spec
from sweep3d.spec.params import Choice, Fixed, Range, Space

__all__ = ["Choice", "ControlInstance", "Fixed", "LoadedSpec", "Range", "Space", "Spec", "load_spec"]
