"""Fixed-structure μ-synthesis: controller structures (tfN, PID, ss:N), the tuning loop, multi-vertex tuning."""
