"""Analyses the docs cite, each run by `protamer analyze NAME` (commands/analyze.py parses their arguments):
they read finished runs and recorded sessions, or train one seed to look inside. They sit above experiments/
(they may import it, human/, agents/, envs/ and view/); nothing below imports them."""
