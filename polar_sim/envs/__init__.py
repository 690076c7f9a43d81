"""polar_sim.envs"""
