"""The composition root: the adapters plugged into the runtime's ports, for ``standoff fly``,
``standoff ground`` and ``standoff agent`` (``parts`` builds what they share)."""
