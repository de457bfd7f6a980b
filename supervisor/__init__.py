"""supervisor package of humanoid-autonomy."""
