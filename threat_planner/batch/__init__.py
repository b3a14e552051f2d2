"""Batch studies (``threat-planner batch``): study, tasks, backends, results; imports core only."""
