"""perception package of humanoid-autonomy."""
