"""The demo: the default simulated scene end to end (its databases and models
made, the services started, touches run and compared with direct contact).
Above the services, beside the benches; the services do not import it."""
