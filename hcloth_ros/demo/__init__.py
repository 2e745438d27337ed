"""Demos: the headless engine demo, the node demo (the README's main job) and its robot."""
