"""ball_balance's controllers for controller_manager_py (plugins registered in setup.py)."""
