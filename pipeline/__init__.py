"""Config, run store and stage orchestration of impactpipe.

The Python API mirrors the command line::

    from impactpipe.pipeline import load_config, run, read_summary
    config = load_config("configs/quickstart.yaml")
    summary = run(config, "runs/quickstart")
    read_summary("runs/quickstart")["M_lr_over_M_T"]
"""

from .config import Config, ConfigError, load_config
from .stages import read_summary, run

__all__ = ["Config", "ConfigError", "load_config", "read_summary", "run"]
