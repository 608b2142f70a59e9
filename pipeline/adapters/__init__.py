"""Stage adapters: each turns the validated config and its derived values into the plain
parameters of one stage library (hydro, handoff, nbody, analysis), runs it and returns the
stage's summary entries.  Only the orchestrator (:mod:`impactpipe.pipeline.stages`) calls them.
"""
