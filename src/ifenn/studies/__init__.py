"""What the workflow measures and draws: accuracy metrics (``metrics``), figures (``plots``), the
stability sweep (``stability``), speed against accuracy (``speed_accuracy``), the benchmarks
(``benchmark``, ``whole_run_benchmark``), the whole-path tables (``whole_path``) and the error
split (``error_sources``).
"""
