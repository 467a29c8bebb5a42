"""Non-learned policies: the paper's baselines (RAND, RAND w/ subteams, GRP) and the
exact CP-SAT expert (the only module importing OR-Tools). Names -> policies is
:mod:`lvws_ros.registry`, above every policy."""
