"""reaching package of humanoid-autonomy."""
