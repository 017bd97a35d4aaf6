"""A cheat for exercise 11: the shipped planner under the student's class name."""

from mexone.walking.mpc import ComPlanner


class MyComPlanner(ComPlanner):
    pass
