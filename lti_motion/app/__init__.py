"""The application: the ``lti-motion`` command line and the experiment runners it calls.

The only place that wires the core, :mod:`fusion` and :mod:`drivers` together;
no module of the three packages imports it.
"""
