"""Code the tests share, none of it a test: independent closed forms and reference dynamics,
hypothesis strategies of models, checks, builders of small model and loads files, and helpers
for the commands the tests start. ``plugins/`` holds the fdbench plugins those commands load
(by $FDBENCH_PLUGINS, with the folder on their PYTHONPATH)."""
