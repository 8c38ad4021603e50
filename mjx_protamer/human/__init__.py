"""The human side: feedback events, the queue, credit assignment, reward models, teachers."""
