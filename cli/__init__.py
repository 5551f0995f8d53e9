"""What the four scripts share: their flags, the run's configuration, one-line errors, the hints.

    cli.train      train_static.py / train_hebb.py: start and resume
    cli.evaluate   evaluate_static.py / evaluate_hebb.py
    cli.flags      the flags, made from the settings' declarations (``settings``)
    cli.config     the run's settings joined, read from config.json and experiment files
    cli.hints      the commands printed for the user (resume, evaluate)
    cli.errors     UserError and the one-line, exit-code-2 report of what a user can get wrong
"""

from cli.errors import Parser, UserError
from cli.evaluate import evaluate_main, evaluation_parser
from cli.flags import flag_table, flag_value
from cli.train import train_main, training_parser

__all__ = ["Parser", "UserError", "evaluate_main", "evaluation_parser", "flag_table", "flag_value", "train_main",
           "training_parser"]
