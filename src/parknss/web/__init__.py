"""The interactive browser view of the closed-loop parking simulator (``parknss web``)."""
