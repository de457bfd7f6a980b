"""model package of humanoid-autonomy."""
