"""footsteps package of humanoid-autonomy."""
