"""The live view of a session in the browser (``telethermal view``)."""
