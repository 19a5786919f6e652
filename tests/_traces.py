"""Code for the scripts tests run in new processes to see what JAX traced there, from JAX's
own compile events (`jax.monitoring`), never from timings."""

# `traced`: the names of the functions JAX traced; `record` is registered by the script
# (`monitoring.register_event_time_span_listener(record)`) where its counting should begin.
RECORD_TRACES = """
from jax import monitoring

traced = []
def record(event, start, end, **kwargs):
    if event == "/jax/core/compile/jaxpr_trace_duration":
        traced.append(kwargs.get("fun_name"))
"""

# A command line run from Python (its arguments those of the script): prints
# `{"code": exit code, "traced": [names]}` as its last line.
TRACED_COMMAND = (
    RECORD_TRACES
    + """
import json, sys
monitoring.register_event_time_span_listener(record)

from jaxdeploy.cli import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "traced": traced}))
"""
)
