"""assist: rider-assistance algorithms (observers, controllers, risk warning, diagnosis) for ptw_env vehicles."""
