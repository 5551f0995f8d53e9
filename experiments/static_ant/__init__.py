"""What makes a static ant stand: the paper's static ant with one of its settings changed at a time.

Each ``*.toml`` here is a variant file of ``experiments/paper/ant_static.toml`` (``paper.py ant static --variant
FILE``): the settings it changes, a short run (20 generations) and a short evaluation (20 episodes per body). The
campaign trains each over three seeds; ``experiments/stand.py`` compares them with the paper's own runs'
first 20 generations, from the runs' files (``results/paper/STATIC_ANT.md``).

Two of the changes are to the episode, not to a setting: this package's modules register a recipe for the
pyBullet ant (``envs.register_recipe``) that wins over the built-in one, and a variant names the module in
its environment ids (``experiments.static_ant.no_burn_in:AntBulletEnv-v0``), so every worker and a resumed
run import it too.
"""
