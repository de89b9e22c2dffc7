"""One executor for every table and replay: tasks, a results file that makes a run resumable, three backends.

Table I and II (:func:`~sofar_agents.evaluation.sweep.run_sweep`), the multi-agent table
(:func:`~sofar_agents.evaluation.multi_agent.run_multi_agent_table`), the races script
(``eval/multi_agent_races.py``) and the interventions replays
(:func:`~sofar_agents.evaluation.interventions.replay_interventions`) each describe their tasks and their results
file as a :class:`Job` and run through :func:`execute`, so they share one behaviour:

* **Resume**: the tasks whose keys the results file holds are skipped; a task's key holds the configuration hash,
  so a changed configuration never reuses a row.
* **Faults**: a task that raises is counted (``failed``) and logged, a task lost with a worker process that died
  is counted (``missing``); neither is written, so a rerun retries exactly those; :func:`incomplete_message` is
  the error a script logs before it exits with status 1.
* **Shutdown**: workers end with the driver, even when it is killed (SIGKILL, Ctrl-C): no orphan.
* **Backends** (:data:`BACKENDS`): this process (:func:`~sofar_agents.executor.core.run_inline`), worker
  processes (:mod:`~sofar_agents.executor.processes`) or Ray actors (:mod:`~sofar_agents.executor.ray_actors`).

The worker processes are those of :mod:`sofar_agents.worker_processes`, the transport that the training process
pool shares (docs/decisions/one-executor.md says why training shares the transport and not the executor).
"""

from sofar_agents.executor.core import BACKENDS, Job, RunStats, execute, incomplete_message, missing_summary

__all__ = ["BACKENDS", "Job", "RunStats", "execute", "incomplete_message", "missing_summary"]
