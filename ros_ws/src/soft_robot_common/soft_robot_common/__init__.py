"""Node plumbing shared by the soft-robot packages (no algorithms): parameters, clock watch, main()."""

from .clock_watch import SimClockWatch
from .device_paths import PathClaim, namespaced_path
from .diagnostics import NodeDiagnostics
from .message_checks import MessageGate, message_problem
from .node_main import run_node
from .parameters import (ConfigurationError, Param, declare_parameters, params_from_dataclass, topic_name_problem,
                         undeclared_overrides)

__all__ = ["ConfigurationError", "MessageGate", "NodeDiagnostics", "Param", "PathClaim", "SimClockWatch",
           "declare_parameters", "message_problem", "namespaced_path", "params_from_dataclass", "run_node",
           "topic_name_problem", "undeclared_overrides"]
