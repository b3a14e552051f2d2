"""The benchmarks of threat_planner: ``python -m bench SUITE`` from the repository root.

``bench/__main__.py`` holds the registry of suites, ``bench/suites/`` one module a suite and
``bench/toolkit/`` the helpers they share; results go to ``bench/results/``.
"""
