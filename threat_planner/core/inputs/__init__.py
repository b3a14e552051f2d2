"""Settings, PlannerConfig, scenario files: what the user gives (imports: world)."""
