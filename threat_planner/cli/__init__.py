"""Command line ``threat-planner``: plan, paper reproduction, figures and replay."""

from threat_planner.cli.main import build_parser, main

__all__ = ['build_parser', 'main']
