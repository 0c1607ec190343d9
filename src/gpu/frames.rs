//! Frames in flight: each slot owns a command buffer, a fence and a host-visible
//! uniform buffer. `begin` waits only for the fence of the frame that last used the
//! slot (N frames ago), so the CPU records frame f while the GPU still runs f − 1,
//! and a uniform buffer is rewritten only after the GPU has finished reading it
//! (the fence wait is the Vulkan host-access synchronisation, spec §7.9).
#![allow(unsafe_code)]

use super::{vkr, Buffer, GpuContext, GpuError};
use ash::vk;

pub struct FrameSlot<'a> {
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    pub uniform: Buffer<'a>,
}

pub struct FrameRing<'a> {
    ctx: &'a GpuContext,
    slots: Vec<FrameSlot<'a>>,
    next: usize,
}

impl<'a> FrameRing<'a> {
    /// `frames_in_flight` slots with a uniform buffer of `uniform_size` bytes each.
    pub fn new(ctx: &'a GpuContext, frames_in_flight: usize, uniform_size: u64) -> Result<Self, GpuError> {
        let mut ring = Self { ctx, slots: Vec::new(), next: 0 };
        for i in 0..frames_in_flight.max(1) {
            let uniform = Buffer::new(
                ctx,
                uniform_size,
                // Also a copy source: the stereo renderer copies the slot's
                // parameters into a device-local block at the frame's start
                // (VUID-vkCmdCopyBuffer-srcBuffer-00118).
                vk::BufferUsageFlags::UNIFORM_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC,
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                &format!("frame {i} uniforms"),
            )?;
            let cmd = ctx.allocate_command_buffer()?;
            // Created signalled, so the first `begin` of each slot does not wait.
            let info = vk::FenceCreateInfo::default().flags(vk::FenceCreateFlags::SIGNALED);
            // SAFETY: valid device.
            let fence = match unsafe { ctx.device.create_fence(&info, None) } {
                Ok(f) => f,
                Err(r) => {
                    // SAFETY: never submitted.
                    unsafe { ctx.device.free_command_buffers(ctx.command_pool, &[cmd]) };
                    return Err(GpuError::Vk { call: "vkCreateFence", result: r });
                }
            };
            ring.slots.push(FrameSlot { cmd, fence, uniform });
        }
        Ok(ring)
    }

    pub fn frames_in_flight(&self) -> usize {
        self.slots.len()
    }

    pub fn slot(&self, i: usize) -> &FrameSlot<'a> {
        &self.slots[i % self.slots.len()]
    }

    /// Wait until the next slot's previous frame is done, then start recording it.
    /// Returns the slot index and its command buffer.
    pub fn begin(&mut self) -> Result<(usize, vk::CommandBuffer), GpuError> {
        let i = self.next;
        self.next = (self.next + 1) % self.slots.len();
        let s = &self.slots[i];
        let d = &self.ctx.device;
        // SAFETY: the fence and command buffer belong to this device; after the wait
        // the command buffer is no longer pending and may be reset and re-recorded.
        unsafe {
            d.wait_for_fences(&[s.fence], true, u64::MAX).map_err(vkr("wait for frame fence"))?;
            d.reset_fences(&[s.fence]).map_err(vkr("reset frame fence"))?;
            d.reset_command_buffer(s.cmd, vk::CommandBufferResetFlags::empty()).map_err(vkr("reset command buffer"))?;
            d.begin_command_buffer(
                s.cmd,
                &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .map_err(vkr("begin command buffer"))?;
        }
        Ok((i, s.cmd))
    }

    /// End and submit slot `i` (returned by `begin`) without waiting.
    pub fn submit(&self, i: usize) -> Result<(), GpuError> {
        let s = &self.slots[i];
        let d = &self.ctx.device;
        let submit = vk::SubmitInfo::default().command_buffers(std::slice::from_ref(&s.cmd));
        // SAFETY: `cmd` is recording (begun in `begin`); the fence was reset there.
        unsafe {
            d.end_command_buffer(s.cmd).map_err(vkr("end command buffer"))?;
            d.queue_submit(self.ctx.queue, &[submit], s.fence).map_err(vkr("queue submit"))?;
        }
        Ok(())
    }

    /// Wait for every frame in flight.
    pub fn wait_all(&self) -> Result<(), GpuError> {
        let fences: Vec<_> = self.slots.iter().map(|s| s.fence).collect();
        // SAFETY: fences of this device.
        unsafe { self.ctx.device.wait_for_fences(&fences, true, u64::MAX) }.map_err(vkr("wait for frames"))
    }
}

impl Drop for FrameRing<'_> {
    fn drop(&mut self) {
        let _ = self.wait_all();
        // SAFETY: all frames completed; command buffers and fences are idle. The
        // uniform buffers drop after this, with the slots.
        unsafe {
            for s in &self.slots {
                self.ctx.device.free_command_buffers(self.ctx.command_pool, &[s.cmd]);
                self.ctx.device.destroy_fence(s.fence, None);
            }
        }
    }
}
