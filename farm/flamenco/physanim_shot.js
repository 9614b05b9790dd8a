// SPDX-License-Identifier: GPL-3.0-or-later
// Flamenco 3 job type for a PhysAnim shot: one task bakes every PhysAnim system of the scene
// and saves the file (its caches go beside it, '//'-relative, on the shared storage); render
// tasks of `chunk_size` frames wait for it, and each checks the bake before rendering
// (`-c physanim render`). Install: copy this file into the Manager's `scripts/` folder and
// restart it; submit from Blender's Flamenco add-on ("PhysAnim Shot").
// Not run here (no Flamenco Manager on the test machines); the OpenJD templates beside it are.

const JOB_TYPE = {
    label: "PhysAnim Shot",
    description: "Bake PhysAnim (particles, spring meshes, rigid bodies), then render the frames",
    settings: [
        { key: "frames", type: "string", required: true,
          eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'",
          evalInfo: { showLinkButton: true, description: "Scene frame range" },
          description: "Frames to bake and render, A-B" },
        { key: "chunk_size", type: "int32", default: 10,
          description: "Frames each render task renders" },
        { key: "render_output_path", type: "string", subtype: "file_path", editable: false,
          eval: "str(Path(abspath(C.scene.render.filepath)))",
          description: "Render output, '#' for the frame number" },
        { key: "blendfile", type: "string", required: true, visible: "web",
          description: "The shot (saved by the bake task)" },
    ],
};

function compileJob(job) {
    const settings = job.settings;
    const bake = author.Task("physanim-bake", "blender");
    bake.addCommand(author.Command("blender-render", {
        exe: "{blender}",
        exeArgs: "-b -y",
        argsBefore: [],
        blendfile: settings.blendfile,
        args: ["-c", "physanim", "bake", "--frames", settings.frames, "--save"],
    }));
    job.addTask(bake);

    for (const chunk of frameChunker(settings.frames, settings.chunk_size)) {
        const render = author.Task(`render-${chunk}`, "blender");
        render.addCommand(author.Command("blender-render", {
            exe: "{blender}",
            exeArgs: "-b -y",
            argsBefore: [],
            blendfile: settings.blendfile,
            args: ["-c", "physanim", "render", "--frames", chunk,
                   "--output", settings.render_output_path],
        }));
        render.addDependency(bake);
        job.addTask(render);
    }
}
