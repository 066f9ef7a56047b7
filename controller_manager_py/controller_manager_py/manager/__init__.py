"""Manager room: resource manager, controller manager core, loop, statistics, diagnostics."""
