"""Planning in time: threats that move and pop up, timed costs, replans in flight."""
