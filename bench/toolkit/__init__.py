"""Helpers the bench suites share, one module a concern.

* :mod:`.repo`: where the repository, its data and the results are; a suite's command line.
* :mod:`.cases`: the scenarios and generated problems the suites plan.
* :mod:`.checkouts`: the same measurement on two checkouts, taking turns.
* :mod:`.timing`: wall times, sampling, memory and summary statistics.
* :mod:`.report`: Markdown tables and result files.
* :mod:`.grid`, :mod:`.ompl_planners`: the grid floor and OMPL on the planner's own J.
* :mod:`.flight_limits`, :mod:`.yardstick`, :mod:`.yardstick_table`: the yardsticks.
* :mod:`.benchmark_report`: tables, targets and plot of the benchmark suite.
* :mod:`.node`: planner node processes and the ROS client of the node suites.

Nothing is imported here, so that a suite pays only for the modules it uses.
"""
