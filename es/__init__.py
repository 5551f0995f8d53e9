"""The evolution strategy and its distribution: arrays and workers, never an environment, a policy
kind or a script by name.

    loop.py        one generation, top to bottom: ask -> tasks -> evaluate -> fitness -> tell -> record
    strategy.py    the ask/tell interface, and what a strategy declares (its settings, its population rule)
    strategies/    the registry of strategies (--strategy), each in its module with its settings: openai
                   (Salimans et al. 2017, shaping and optimiser injected), pgpe, snes, cma_es, sep_cma_es, ars
    shaping.py     the fitness penalty and the fitness shapings (the original's, OpenAI's, none)
    optimizers.py  the step: the original's SGD, OpenAI's Adam and momentum, weight decay
    observations.py  --obs_norm's running observation statistics (OpenAI's RunningStat) and their files
    settings.py    ESSettings (the search's and every strategy's), RunSettings: the settings as frozen data
    runfolder.py   the files of a run: names, best/last, metrics, the checkpoint
    backends/      serial, process pool, Ray: one Evaluator interface, chunking and retries once
    worker.py      the wire protocol: a task record -> an episode's return, steps and penalty
    noise.py       the shared noise table
    files.py       atomic writes, the original .dat format, safe loading
    interrupts.py  Ctrl-C and SIGTERM: finish the generation, save, stop
"""
