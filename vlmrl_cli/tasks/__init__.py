"""Task plug-ins: everything that knows one environment (its env, milestones, camera, reader)."""
