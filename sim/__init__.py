"""sim package of humanoid-autonomy."""
