"""CAN Workshop 202 on top of the board: the classroom and master console, checks, grading and its sandbox, plots.

May import every other part of appsim.
"""
