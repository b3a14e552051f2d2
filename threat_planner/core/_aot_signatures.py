"""Signatures of the AOT exports, for building the module beside the JIT workload.

Written by ``python -m threat_planner.core.aot_build --signatures``; a test checks
them against the workload's. Each: (return type, argument types), as numba prints them.
"""

F8 = 'float64'
I8 = 'int64'
B1 = 'bool'
NONE = 'none'
A1 = 'array(float64, 1d, C)'
A2 = 'array(float64, 2d, C)'
A3 = 'array(float64, 3d, C)'
R1 = 'readonly array(float64, 1d, C)'
R2 = 'readonly array(float64, 2d, C)'
I1 = 'array(int64, 1d, C)'

SIGNATURES = {
    'threat_planner.core.cost.kernels._kernel':
        (F8, (A2, R2, R1, F8, I1, I1, R1, R1, A2)),
    'threat_planner.core.cost.kernels._segment_costs':
        (NONE, (A2, A2, R2, R1, I1, I1, R1, R1, A1)),
    'threat_planner.core.cost.kernels._segment_costs_parallel':
        (NONE, (A2, A2, R2, R1, R1, R1, A1)),
    'threat_planner.core.cost.kernels._path_threat_cost':
        (F8, (A2, R2, R1, R1, R1)),
    'threat_planner.core.cost.near_kernels._bin':
        ('UniTuple(array(int64, 1d, C) x 2)', (R2, A1, F8, I1)),
    'threat_planner.core.cost.near_kernels._near_costs':
        (NONE, (A2, A2, R2, R1, F8, A1, F8, I1, I1, I1, R1, R1, A1, A1)),
    'threat_planner.core.cost.far_kernels._far_pairs':
        ('UniTuple(array(int64, 1d, C) x 2)', (A2, A2, A2, A2, A1, I1, I1, I8, I8, I8, F8,
         F8)),
    'threat_planner.core.network.graph_kernels._dijkstra':
        (NONE, (I1, I1, A1, I8, I8, A1, I1)),
    'threat_planner.core.network.graph_kernels.incentre_kernel':
        (NONE, (A3, A2, A1)),
    'threat_planner.core.optimise.lbfgs._objective':
        (F8, (A1, I8, R2, R1, F8, I1, I1, R1, R1, F8, F8, F8, A1, A1, F8, A1, A2, A1, A1)),
    'threat_planner.core.optimise.lbfgs.objective_scale':
        (F8, (F8,)),
    'threat_planner.core.optimise.lbfgs._minimise':
        ('Tuple(float64, int64, int64, int64)', (A1, A1, A1, R2, R1, F8, I1, I1, R1, R1, F8,
         F8, F8, A1, A1, F8, A1, A2, I8, F8, F8, I8, F8, B1, F8, A1, A1)),
    'threat_planner.core.optimise.limit_kernels._measure':
        ('UniTuple(float64 x 4)', (A2, F8)),
    'threat_planner.core.optimise.limit_kernels._values':
        (I8, (A2, F8, F8, F8, B1, B1, B1, A1)),
    'threat_planner.core.optimise.limit_kernels._penalty':
        ('Tuple(float64, int64)', (A2, F8, F8, F8, B1, B1, B1, A1, F8, A1, A2)),
    'threat_planner.core.optimise.limit_kernels._jacobian':
        (I8, (A2, F8, F8, F8, B1, B1, B1, A1, A3)),
    'threat_planner.core.optimise.lagrangian_kernels._rounds':
        (I8, (A1, A1, A1, R2, R1, F8, I1, I1, R1, R1, F8, F8, F8, A1, A1, I8, F8, F8, I8, F8,
         B1, I8, F8, F8, F8, A1, F8, A1, F8, A1, A1, A2)),
    'threat_planner.core.optimise.chain_kernels._integrate':
        ('Tuple(int64, bool)', (A2, R2, R1, F8, F8, F8, F8, F8, F8, F8, F8, F8, I8, A1, A1,
         B1)),
    'threat_planner.core.optimise.chain_kernels._resample':
        (NONE, (A2, I8, A2)),
}
