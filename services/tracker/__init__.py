"""Tracker service: motion capture in, marker poses and the robot's position out."""
