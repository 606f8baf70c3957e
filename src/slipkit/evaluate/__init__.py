"""Metrics, detection latency, ROC and the tables and plots written into run folders."""
