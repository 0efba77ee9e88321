"""Node plumbing shared by the soft-robot packages (no algorithms): parameters, clock watch, main()."""

from .clock_watch import SimClockWatch
from .device_paths import PathClaim, namespaced_path
from .node_main import run_node
from .parameters import ConfigurationError, Param, declare_parameters, params_from_dataclass, undeclared_overrides

__all__ = ["ConfigurationError", "Param", "PathClaim", "SimClockWatch", "namespaced_path", "declare_parameters", "params_from_dataclass",
           "run_node", "undeclared_overrides"]
