-- Scenes of several objects (issue 19): the name of the object a skill grasped, when its
-- session names its objects (a scene given as a list of `objects`, or a named `object`);
-- NULL for a session's one unnamed object, as for every skill stored before this migration
-- (their sessions held one object: NULL says the same).
ALTER TABLE skills ADD COLUMN object_name TEXT;
