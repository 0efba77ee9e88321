"""Node plumbing shared by the soft-robot packages (no algorithms): parameters and main()."""

from .node_main import ConfigurationError, declare_parameters, run_node

__all__ = ["ConfigurationError", "declare_parameters", "run_node"]
