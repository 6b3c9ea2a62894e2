"""The six tasks' names and titles, in the paper's order (docs/method.md §3).

The one list of tasks: the task classes take their titles from here, and the command line reads
it without importing the simulator (its help texts are built before any command runs).
"""

TITLES = {"balancing": "Balancing", "landing": "Landing", "crawling": "Crawling",
          "hurdling": "Hurdling", "gripping": "Gripping", "box": "Moving a box"}
NAMES = tuple(TITLES)
N_STEPS = 100  # every task's episode: 100 control steps (of the simulator's substeps)
