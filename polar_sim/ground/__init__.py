"""polar_sim.ground"""
