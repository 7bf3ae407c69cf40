"""Reading results: frequency responses, chirp envelopes, CSV and plots."""
