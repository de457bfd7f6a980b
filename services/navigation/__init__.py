"""navigation package of humanoid-autonomy."""
