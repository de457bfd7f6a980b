"""ik package of humanoid-autonomy."""
