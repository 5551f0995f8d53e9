"""What the four scripts share: their flags, the run's configuration, one-line errors, the hints.

    cli.train      train_static.py / train_hebb.py: flags, config, start and resume
    cli.evaluate   evaluate_static.py / evaluate_hebb.py
    cli.config     the run's settings joined (config.json, experiment files)
    cli.hints      the commands printed for the user (resume, evaluate)
    cli.errors     UserError and the one-line, exit-code-2 report of what a user can get wrong
"""

from cli.errors import Parser, UserError
from cli.evaluate import evaluate_main, evaluation_parser
from cli.flags import flag_value
from cli.train import train_main, training_parser
from policies import DISTRIBUTIONS, INIT_CHOICES, RULES

__all__ = ["DISTRIBUTIONS", "INIT_CHOICES", "RULES", "Parser", "UserError", "evaluate_main", "evaluation_parser",
           "flag_value", "train_main", "training_parser"]
