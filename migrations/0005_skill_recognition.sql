-- The assistant (issue 20): what recognising a skill early needs, and what on-line learning
-- linked a skill to.
--
-- `approach`: the skill's approach template (services::assist::features): TEMPLATE_DIM
-- little-endian f32, NaN where the reach did not show a value; NULL where it was not computed:
-- skills stored before this migration (`icms reprocess` computes them: the segmentation
-- version rose to 2 with it, and a skill that comes out the same keeps its id and replays and
-- gets its template), and skills of a session whose hand model is not known.
ALTER TABLE skills ADD COLUMN approach BLOB;
-- `matched_skill_id`: the stored skill this one was recognised as when it was stored (the
-- nearest of the recognised kind by the feature distance `similar` uses); NULL for a skill
-- stored as new (nothing stored fitted), and for skills stored before this migration.
ALTER TABLE skills ADD COLUMN matched_skill_id INTEGER REFERENCES skills (id) ON DELETE SET NULL;
