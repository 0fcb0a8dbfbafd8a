"""The application layer: the robot as a library (see robot.py). Below the CLI, the fleet
agent and the pytest plugin; it never prints, prompts or exits."""
