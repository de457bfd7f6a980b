"""walking package of humanoid-autonomy."""
