"""bus package of humanoid-autonomy."""
