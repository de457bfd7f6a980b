"""humanoid-autonomy: services (bus adapters) and the pure algorithm packages they wrap."""
