"""Control: PID heat-flux loop and the safety supervisor (time always injected)."""
