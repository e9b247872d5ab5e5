"""Many runs: a sweep of (arm, seed) jobs, its workers, leases, executors, checks and cost."""
