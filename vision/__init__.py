"""vision package of humanoid-autonomy."""
